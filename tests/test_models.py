"""robots.models: loaders, standing configurations, point frames, missing files."""

import importlib.metadata

import numpy as np
import pinocchio as pin
import pytest

import prioik.robots.models as models
from prioik.robots import ModelNotFoundError, g1, load, sample_humanoid, spatial_chain, talos


@pytest.fixture(scope="module")
def g1_robot():
    return g1()


def test_g1_has_29_joints_floating_base_and_stands_on_its_feet(g1_robot):
    r = g1_robot
    assert (r.nq, r.nv, r.n_base) == (36, 35, 6)
    lo, hi, vmax = r.joint_limits()
    assert lo.shape == hi.shape == vmax.shape == (29,)
    assert np.all(lo < r.q0[7:]) and np.all(r.q0[7:] < hi)
    assert np.all(np.isfinite(vmax)) and np.all(vmax > 0)
    d = r.data()
    pin.framesForwardKinematics(r.model, d, r.q0)
    for foot in ("left_foot", "right_foot"):
        assert abs(d.oMf[r.frame_id(foot)].translation[2]) < 1e-12
    # feet symmetric about the sagittal plane, hands above the feet
    yl = d.oMf[r.frame_id("left_foot")].translation[1]
    yr = d.oMf[r.frame_id("right_foot")].translation[1]
    assert yl == pytest.approx(-yr, abs=1e-9) and yl > 0.05
    assert d.oMf[r.frame_id("left_hand")].translation[2] > 0.4


def test_g1_file_is_found_from_the_installed_distribution(g1_robot):
    root = models.example_robot_data_dir()
    assert root.name == "robots" and root.is_dir()
    assert g1_robot.source == str(root / models.G1_URDF)
    dist = importlib.metadata.distribution("example-robot-data")
    assert str(root).startswith(str(dist.locate_file("")))


def test_talos_reduced_locks_grippers_and_head():
    r = talos()
    assert r.nv == 38 - 4 and r.nq == r.nv + 1
    names = list(r.model.names)
    assert "gripper_left_joint" not in names and "head_1_joint" not in names
    lo, hi, _ = r.joint_limits()
    assert np.all(lo <= r.q0[7:] + 1e-12) and np.all(r.q0[7:] <= hi + 1e-12)


def test_sample_humanoid_needs_no_files():
    r = sample_humanoid()
    assert r.nv == 34 and r.floating_base
    for role in ("left_foot", "right_foot", "left_hand", "right_hand"):
        r.frame_id(role)


@pytest.mark.parametrize("n", [1, 2, 7, 30])
def test_spatial_chain_of_any_length(n):
    r = spatial_chain(n)
    assert r.nq == r.nv == n and r.n_base == 0
    d = r.data()
    pin.framesForwardKinematics(r.model, d, r.q0)
    # the tip is 0.3 m from the last joint; with all joints at 0 the chain is straight
    pin.framesForwardKinematics(r.model, d, np.zeros(n))
    assert d.oMf[r.frame_id("tip")].translation == pytest.approx([0.3 * n, 0, 0], abs=1e-12)
    assert load(f"chain{n}").nv == n


def test_spatial_chain_rejects_bad_length():
    with pytest.raises(ValueError, match="n_links"):
        spatial_chain(0)


def test_point_frame_is_added_to_a_copy(g1_robot):
    r = g1_robot
    before = r.model.nframes
    r2 = r.with_point_frame("sword_tip", "left_hand", (0.5, 0.0, 0.0))
    assert r.model.nframes == before and not r.model.existFrame("sword_tip")
    assert r2.model.nframes == before + 1
    d = r2.data()
    pin.framesForwardKinematics(r2.model, d, r2.q0)
    hand = d.oMf[r2.frame_id("left_hand")]
    tip = d.oMf[r2.frame_id("sword_tip")].translation
    assert tip == pytest.approx(hand.act(np.array([0.5, 0.0, 0.0])), abs=1e-12)
    assert np.linalg.norm(tip - hand.translation) == pytest.approx(0.5, abs=1e-12)
    with pytest.raises(ValueError, match="already has a frame"):
        r2.with_point_frame("sword_tip", "left_hand", (0.1, 0, 0))


def test_unknown_frame_and_robot_are_named():
    r = spatial_chain(3)
    with pytest.raises(KeyError, match="no_such_frame"):
        r.frame_id("no_such_frame")
    with pytest.raises(ValueError, match="unknown robot 'atlas'"):
        load("atlas")


def test_missing_package_gives_a_clear_error(monkeypatch):
    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)
    monkeypatch.setattr(models.importlib.metadata, "distribution", missing)
    with pytest.raises(ModelNotFoundError, match=r"example-robot-data \(the `robots` extra\); "
                                                 r"install it with `pip install prioik\[robots\]`"):
        g1()


def test_missing_file_gives_a_clear_error(monkeypatch):
    monkeypatch.setattr(models, "G1_URDF", "g1_description/urdf/no_such_robot.urdf")
    with pytest.raises(ModelNotFoundError, match="no_such_robot.urdf"):
        g1()


def test_with_armature_adds_rotor_inertia_to_the_actuated_diagonal_only():
    robot = sample_humanoid()
    heavy = robot.with_armature(0.1)
    M0 = pin.crba(robot.model, robot.data(), robot.q0)
    M1 = pin.crba(heavy.model, heavy.data(), heavy.q0)
    nb = robot.n_base
    expected = np.zeros(robot.nv)
    expected[nb:] = 0.1
    np.testing.assert_allclose(np.diag(M1 - M0), expected, atol=1e-12)
    np.testing.assert_allclose(np.triu(M1 - M0, 1), 0.0, atol=1e-12)
    assert np.all(np.asarray(robot.model.armature) == 0.0)    # the original is untouched
    with pytest.raises(ValueError, match="armature"):
        robot.with_armature(-1.0)


# ------------------------------------------------------------------ any robot: from_urdf
from prioik.robots import (  # noqa: E402
    KinematicState,
    RobotModel,
    from_urdf,
    go2,
    joint_limit_bounds,
    panda,
    posture,
    solo12,
    ur5,
)
from prioik.robots.models import PANDA_FINGERS  # noqa: E402

_LINK = ('<link name="{0}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" '
         'iyy="1" iyz="0" izz="1"/></inertial></link>')
_REVOLUTE = ('<joint name="{0}" type="revolute"><parent link="{1}"/><child link="{2}"/>'
             '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="2"/></joint>')


def _urdf(tmp_path, root_joint: str | None) -> str:
    """A two-link URDF; ``root_joint`` ``"floating"`` or ``"fixed"`` attaches ``base`` to
    a ``world`` link with that joint type, ``None`` leaves ``base`` the root."""
    body = [_LINK.format("base"), _LINK.format("l1"), _REVOLUTE.format("j1", "base", "l1")]
    if root_joint is not None:
        body = ['<link name="world"/>',
                f'<joint name="root" type="{root_joint}"><parent link="world"/>'
                '<child link="base"/></joint>'] + body
    path = tmp_path / f"r_{root_joint}.urdf"
    path.write_text('<robot name="two">' + "".join(body) + "</robot>")
    return str(path)


def test_panda_is_fixed_base_and_posture_and_limits_cover_every_joint():
    r = panda()
    assert (r.nq, r.nv, r.n_base, r.floating_base) == (9, 9, 0, False)
    lo, hi, vmax = r.joint_limits()
    assert lo.shape == (9,)
    # the 7 arm joints' URDF limits, then the two fingers' [0, 0.04] m
    assert lo[3] == pytest.approx(-3.0718) and hi[5] == pytest.approx(3.7525)
    assert np.allclose(lo[7:], 0.0) and np.allclose(hi[7:], 0.04)
    assert np.all(lo <= r.q0) and np.all(r.q0 <= hi)
    state = KinematicState(r, r.q0, np.zeros(9), drift=False)
    assert np.array_equal(posture(state, r.q0).J, np.eye(9))
    bounds = joint_limit_bounds(state, 0.1, 0.01)
    assert np.array_equal(bounds.A, np.eye(9))
    assert np.all(np.isfinite(bounds.lower)) and np.all(np.isfinite(bounds.upper))


def test_panda_arm_without_fingers_by_locking_them():
    path = models.example_robot_data_dir() / models.PANDA_URDF
    arm = from_urdf(path, locked_joints=PANDA_FINGERS,
                    srdf=models.example_robot_data_dir() / models.PANDA_SRDF)
    full = panda()
    assert (arm.nv, arm.n_base) == (7, 0)
    assert np.array_equal(arm.q0, full.q0[:7])
    d_arm, d_full = arm.data(), full.data()
    pin.framesForwardKinematics(arm.model, d_arm, arm.q0)
    pin.framesForwardKinematics(full.model, d_full, full.q0)
    f = "panda_hand"
    assert np.allclose(d_arm.oMf[arm.frame_id(f)].homogeneous,
                       d_full.oMf[full.frame_id(f)].homogeneous, atol=1e-12)


def test_hand_built_robot_reads_its_base_from_the_model():
    """The old default (floating) silently dropped the Panda's joints 1-6."""
    p = panda()
    r = RobotModel("mine", p.model, p.q0)
    assert not r.floating_base and r.n_base == 0 and r.joint_limits()[0].size == 9
    with pytest.raises(ValueError, match="floating_base=True contradicts the model"):
        RobotModel("mine", p.model, p.q0, floating_base=True)
    h = sample_humanoid()
    assert RobotModel("h", h.model, h.q0).floating_base
    with pytest.raises(ValueError, match="floating_base=False contradicts the model"):
        RobotModel("h", h.model, h.q0, floating_base=False)
    with pytest.raises(ValueError, match="q0 must be 9 finite"):
        RobotModel("mine", p.model, np.zeros(8))


@pytest.mark.parametrize("loader", [go2, solo12])
def test_quadrupeds_have_a_free_flyer_and_stand_on_four_feet(loader):
    r = loader()
    assert (r.nq, r.nv, r.n_base, r.floating_base) == (19, 18, 6, True)
    assert r.model.names[1] == "root_joint"
    lo, hi, _ = r.joint_limits()
    assert lo.shape == (12,) and np.all(lo <= r.q0[7:]) and np.all(r.q0[7:] <= hi)
    d = r.data()
    pin.framesForwardKinematics(r.model, d, r.q0)
    z = [d.oMf[r.frame_id(f)].translation[2] for f in r.frames if f.endswith("foot")]
    assert len(z) == 4 and min(z) == pytest.approx(0.0, abs=1e-12) and max(z) < 0.02
    state = KinematicState(r, r.q0, np.zeros(18), drift=False)
    J = posture(state, r.q0).J
    assert J.shape == (12, 18) and np.array_equal(J[:, 6:], np.eye(12)) and not J[:, :6].any()


def test_ur5_is_fixed_to_the_world_by_its_urdf():
    r = ur5()
    assert (r.nv, r.n_base) == (6, 0)
    with pytest.raises(ValueError, match="root link is 'world'"):
        from_urdf(r.source, floating_base=True)


def test_floating_base_is_detected_from_a_floating_root_joint(tmp_path):
    r = from_urdf(_urdf(tmp_path, "floating"))
    assert r.floating_base and (r.nq, r.nv) == (8, 7) and r.joint_limits()[0].size == 1
    assert from_urdf(_urdf(tmp_path, "floating"), floating_base=True).nv == 7
    with pytest.raises(ValueError, match="joint 'root' is of type floating"):
        from_urdf(_urdf(tmp_path, "floating"), floating_base=False)
    fixed = from_urdf(_urdf(tmp_path, "fixed"))
    assert not fixed.floating_base and fixed.nv == 1


def test_undeclared_base_is_fixed_unless_asked_or_the_srdf_says(tmp_path):
    plain = _urdf(tmp_path, None)
    assert from_urdf(plain).nv == 1
    assert from_urdf(plain, floating_base=True).nv == 7
    root = models.example_robot_data_dir()
    urdf, srdf = root / models.GO2_URDF, root / models.GO2_SRDF
    assert from_urdf(urdf).nv == 12                     # the URDF alone does not say
    assert from_urdf(urdf, srdf=srdf).nv == 18          # the SRDF's virtual joint does
    with pytest.raises(ValueError, match="virtual joint 'root_joint' is of type floating"):
        from_urdf(urdf, srdf=srdf, floating_base=False)


def test_load_takes_a_path_with_options(tmp_path):
    plain = _urdf(tmp_path, None)
    import pathlib
    assert load(plain).nv == 1
    assert load(pathlib.Path(plain), floating_base=True).nv == 7
    assert load("panda").nv == 9
    with pytest.raises(ValueError, match="are for a URDF path"):
        load("panda", floating_base=False)
    with pytest.raises(ModelNotFoundError, match="nowhere.urdf"):
        load(str(tmp_path / "nowhere.urdf"))


def test_from_urdf_names_bad_arguments(tmp_path):
    plain = _urdf(tmp_path, None)
    with pytest.raises(KeyError, match="no frame 'tool0'.*role 'tool'"):
        from_urdf(plain, frames={"tool": "tool0"})
    with pytest.raises(ValueError, match="q0 must be 1 finite"):
        from_urdf(plain, q0=[0.0, 1.0])
    with pytest.raises(KeyError, match="no joint 'elbow'"):
        from_urdf(plain, q0={"elbow": 0.3})
    assert from_urdf(plain, q0={"j1": 0.3}).q0 == pytest.approx([0.3])
    with pytest.raises(KeyError, match="no group state 'standing'"):
        from_urdf(plain, q0="standing")
    with pytest.raises(KeyError, match="cannot lock joint 'j9'"):
        from_urdf(plain, locked_joints=["j9"])
    with pytest.raises(ModelNotFoundError, match="package dir"):
        from_urdf(plain, package_dirs=[tmp_path / "missing"])
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot")
    with pytest.raises(ValueError, match="not valid XML"):
        from_urdf(bad)
    with pytest.raises(ValueError, match="base quaternion"):
        from_urdf(plain, floating_base=True, q0=np.zeros(8))


def test_state_sizes_follow_a_replaced_model():
    """The cached sizes and unit-norm parts (read every control step) are those of the
    model the robot holds now."""
    robot = spatial_chain(3)
    assert (robot.nq, robot.nv) == (3, 3) and robot.state_sizes()[3].size == 0
    robot.model = sample_humanoid().model          # a free flyer: a quaternion at q[3:7]
    nq, nv = robot.model.nq, robot.model.nv
    assert (robot.nq, robot.nv) == (nq, nv)
    assert robot.state_sizes()[3].tolist() == [3, 4]
    q = pin.neutral(robot.model)
    q[3:7] = 0.0
    with pytest.raises(models.StateError, match="quaternion"):
        KinematicState(robot, q, np.zeros(nv))
