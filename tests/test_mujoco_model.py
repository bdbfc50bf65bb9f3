"""robots.mujoco_model: the URDF as MuJoCo reads it, and q <-> qpos giving the same frame
positions as pinocchio at random configurations (fixed and floating base)."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from prioik.robots import load
from prioik.robots.mujoco_model import (
    COMPILER,
    MujocoModelError,
    body_positions,
    frame_positions,
    mujoco_urdf,
    to_mujoco,
)


def test_the_urdf_loses_its_geometry_and_mimics_and_gains_the_compiler():
    text = (
        '<robot name="r"><mujoco><compiler angle="degree"/></mujoco>'
        '<link name="a"><visual/><collision/><inertial/></link><link name="b"/>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
        '<mimic joint="k"/></joint></robot>')
    out = mujoco_urdf(text)
    for tag in ("<visual", "<collision", "<mimic", 'angle="degree"'):
        assert tag not in out
    assert out.count("<mujoco>") == 1 and "<inertial" in out
    for key, value in COMPILER.items():
        assert f'{key}="{value}"' in out
    with pytest.raises(MujocoModelError, match="not valid XML"):
        mujoco_urdf("<robot")
    with pytest.raises(MujocoModelError, match="not <robot>"):
        mujoco_urdf("<sdf/>")


def _random_configuration(robot, rng):
    lo, hi, _ = robot.joint_limits()
    q = robot.q0.copy()
    idx = robot.actuated_q_index()
    q[idx] = rng.uniform(lo, hi)
    if robot.floating_base:
        q[:3] = rng.uniform(-1.0, 1.0, 3)
        quat = rng.standard_normal(4)
        q[3:7] = quat / np.linalg.norm(quat)
    return q


@pytest.mark.parametrize("name, floating", [("panda", False), ("g1", True)])
def test_every_body_is_where_pinocchio_puts_its_frame(name, floating):
    robot = load(name)
    mj = to_mujoco(robot)
    assert robot.floating_base is floating and (mj.free_joint is not None) is floating
    assert mj.model.nv == robot.nv
    assert mj.joint_names == list(robot.model.names)[1:]
    bodies = [mj.model.body(i).name for i in range(1, mj.model.nbody)]
    assert {robot.frames[k] for k in ("hand", "tcp") if k in robot.frames} <= set(bodies)
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = _random_configuration(robot, rng)
        assert np.max(np.abs(body_positions(mj, q, bodies)
                             - frame_positions(robot, q, bodies))) <= 1e-9
        np.testing.assert_allclose(mj.to_q(mj.to_qpos(q)), q, atol=1e-12)
    if floating:      # MuJoCo's quaternion is (w, x, y, z), pinocchio's (x, y, z, w)
        qpos = mj.to_qpos(q)
        np.testing.assert_array_equal(qpos[3:7], q[[6, 3, 4, 5]])


def test_centre_of_mass_matches_pinocchio():
    robot = load("g1")
    mj = to_mujoco(robot)
    q = _random_configuration(robot, np.random.default_rng(3))
    data = mujoco.MjData(mj.model)
    data.qpos[:] = mj.to_qpos(q)
    mujoco.mj_kinematics(mj.model, data)
    mujoco.mj_comPos(mj.model, data)
    com = pin.centerOfMass(robot.model, robot.model.createData(), q)
    assert np.max(np.abs(data.subtree_com[1] - com)) <= 1e-9


def test_a_joint_only_one_model_has_is_named():
    from prioik.robots.arm import ArmScenario
    text = ArmScenario().urdf_text()       # the fingers fixed; joints in load("panda")
    only = r"only in pinocchio \['panda_finger_joint1', 'panda_finger_joint2'\], only in MuJoCo"
    with pytest.raises(MujocoModelError, match=only + " none"):
        to_mujoco(load("panda"), text)
