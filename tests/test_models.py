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
